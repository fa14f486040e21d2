// terrainnet studio: the page. Strokes are drawn here and sent to the worker (worker.js), where
// terrainnet.h compiled to WebAssembly turns them into terrain with the library's default sketch
// path (tn_gnn_generate). index.html?selftest=1 runs the self-test (docs/studio.md).
/* global View3D */
'use strict';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);

// ---- the worker ------------------------------------------------------------------------------
// Cancel ends the worker (a C call cannot be interrupted) and starts a fresh one with the style
// loaded again, so every command in flight fails with 'cancelled'.
let worker = null;
let nextId = 1;
const pending = new Map();
let onProgress = null;
function startWorker() {
    worker = new Worker('worker.js');
    worker.onmessage = (e) => {
        const m = e.data;
        if (m.progress !== undefined) { if (onProgress) onProgress(m.stage, m.progress); return; }
        const p = pending.get(m.id);
        pending.delete(m.id);
        if (m.ok) p.resolve(m); else p.reject(new Error(m.error));
    };
    worker.onerror = (e) => { status('worker error: ' + (e.message || e)); };
}
startWorker();
function ask(cmd, args, transfer) {
    const id = nextId++;
    return new Promise((resolve, reject) => {
        pending.set(id, { resolve, reject });
        worker.postMessage(Object.assign({ id: id, cmd: cmd }, args), transfer || []);
    });
}
let busy = 0; // commands the Cancel button can stop (generate, learn)
function setBusy(delta) {
    busy += delta;
    $('cancel').disabled = busy <= 0;
}
async function cancel() {
    worker.terminate();
    for (const p of pending.values()) p.reject(new Error('cancelled'));
    pending.clear();
    onProgress = null;
    startWorker();
    if (styleBytes) await loadStyle(style, styleBytes.slice().buffer);
    await warmup();
}

function status(text) { $('status').textContent = text; }
function bar(f) { $('bar').style.width = (100 * Math.max(0, Math.min(1, f))).toFixed(1) + '%'; }

// ---- the sketch: strokes of (x, y, height) on a canvas of canvasW x canvasH sketch pixels ----
const sketch = { canvasW: 256, canvasH: 256, strokes: [] };
const undoStack = [];
let tool = 'ridge';
let current = null;      // the stroke being drawn
let background = null;   // the last hillshade, under the strokes
const draw = $('draw'), dctx = draw.getContext('2d');

function snapshot() {
    undoStack.push(JSON.stringify(sketch));
    if (undoStack.length > 200) undoStack.shift();
}
function undo() {
    if (!undoStack.length) return;
    Object.assign(sketch, JSON.parse(undoStack.pop()));
    redraw();
}
function toSketch(e) {
    const r = draw.getBoundingClientRect();
    return [(e.clientX - r.left) / r.width * sketch.canvasW - 0.5, (e.clientY - r.top) / r.height * sketch.canvasH - 0.5];
}
function strokeColour(type, h) { // a drawing's convention: red ridges, blue valleys, brightness = height
    const v = Math.round(90 + 165 * h);
    return type === 'ridge' ? `rgb(${v},30,20)` : `rgb(20,40,${v})`;
}
function redraw() {
    const sx = draw.width / sketch.canvasW, sy = draw.height / sketch.canvasH;
    dctx.fillStyle = '#f4f1ea';
    dctx.fillRect(0, 0, draw.width, draw.height);
    if (background) {
        dctx.globalAlpha = 0.45;
        dctx.drawImage(background, 0, 0, draw.width, draw.height);
        dctx.globalAlpha = 1;
    }
    dctx.lineCap = 'round';
    dctx.lineJoin = 'round';
    for (const s of sketch.strokes.concat(current ? [current] : [])) {
        dctx.lineWidth = 4;
        for (let i = 1; i < s.pts.length; i++) {
            const a = s.pts[i - 1], b = s.pts[i];
            dctx.strokeStyle = strokeColour(s.type, 0.5 * (a[2] + b[2]));
            dctx.beginPath();
            dctx.moveTo((a[0] + 0.5) * sx, (a[1] + 0.5) * sy);
            dctx.lineTo((b[0] + 0.5) * sx, (b[1] + 0.5) * sy);
            dctx.stroke();
        }
    }
}
// heights along the stroke: start height to end height by arc length
function setHeights(s, h0, h1) {
    let total = 0;
    const acc = [0];
    for (let i = 1; i < s.pts.length; i++) {
        total += Math.hypot(s.pts[i][0] - s.pts[i - 1][0], s.pts[i][1] - s.pts[i - 1][1]);
        acc.push(total);
    }
    for (let i = 0; i < s.pts.length; i++) s.pts[i][2] = total > 0 ? h0 + (h1 - h0) * acc[i] / total : h0;
}
function eraseAt(p) {
    const r = 6 * sketch.canvasW / 256;
    const keep = sketch.strokes.filter((s) => !s.pts.some((q) => Math.hypot(q[0] - p[0], q[1] - p[1]) < r));
    if (keep.length !== sketch.strokes.length) {
        sketch.strokes = keep;
        redraw();
    }
}
draw.addEventListener('pointerdown', (e) => {
    draw.setPointerCapture(e.pointerId);
    const p = toSketch(e);
    snapshot();
    if (tool === 'erase') { eraseAt(p); current = { erase: true }; return; }
    current = { type: tool, pts: [[p[0], p[1], 0]] };
    setHeights(current, +$('h0').value, +$('h1').value);
    redraw();
});
draw.addEventListener('pointermove', (e) => {
    if (!current) return;
    const p = toSketch(e);
    if (current.erase) { eraseAt(p); return; }
    const last = current.pts[current.pts.length - 1];
    if (Math.hypot(p[0] - last[0], p[1] - last[1]) < 2) return; // a point every 2 sketch px
    current.pts.push([Math.max(0, Math.min(sketch.canvasW - 1, p[0])), Math.max(0, Math.min(sketch.canvasH - 1, p[1])), 0]);
    setHeights(current, +$('h0').value, +$('h1').value);
    redraw();
});
function endStroke() {
    if (!current) return;
    if (!current.erase) {
        if (current.pts.length >= 2) sketch.strokes.push(current);
        else undoStack.pop(); // a click draws nothing
    }
    current = null;
    redraw();
}
draw.addEventListener('pointerup', endStroke);
draw.addEventListener('pointercancel', endStroke);

function setTool(t) {
    tool = t;
    for (const n of ['ridge', 'valley', 'erase']) $('tool-' + n).classList.toggle('on', n === t);
}
$('tool-ridge').onclick = () => setTool('ridge');
$('tool-valley').onclick = () => setTool('valley');
$('tool-erase').onclick = () => setTool('erase');
$('undo').onclick = undo;
$('clear').onclick = () => { snapshot(); sketch.strokes = []; redraw(); };
for (const id of ['h0', 'h1']) {
    const show = () => { $(id + 'v').textContent = (+$(id).value).toFixed(2); };
    $(id).oninput = show;
    show();
}
document.addEventListener('keydown', (e) => {
    if (e.target.tagName === 'INPUT' || e.target.tagName === 'SELECT') return;
    if ((e.ctrlKey || e.metaKey) && e.key === 'z') { e.preventDefault(); undo(); }
    else if (e.key === 'r') setTool('ridge');
    else if (e.key === 'v') setTool('valley');
    else if (e.key === 'e') setTool('erase');
});

// .tns text (docs/sketch.md) <-> strokes
function toTns() {
    const lines = ['terrainnet-sketch 1', '# drawn in terrainnet studio', `canvas ${sketch.canvasW} ${sketch.canvasH}`];
    for (const s of sketch.strokes) {
        lines.push(s.type);
        for (const p of s.pts) lines.push(`${+p[0].toFixed(3)} ${+p[1].toFixed(3)} ${+p[2].toFixed(4)}`);
        lines.push('end');
    }
    return lines.join('\n') + '\n';
}
// parses what tn_sketch_format writes (the worker rewrites any .tns or drawing that way first)
function fromTns(text) {
    const out = { canvasW: 256, canvasH: 256, strokes: [] };
    let s = null;
    for (const raw of text.split('\n')) {
        const line = raw.replace(/#.*/, '').trim();
        if (!line) continue;
        const w = line.split(/\s+/);
        if (w[0] === 'canvas') { out.canvasW = +w[1]; out.canvasH = +w[2]; }
        else if (w[0] === 'ridge' || w[0] === 'valley') s = { type: w[0], pts: [] };
        else if (w[0] === 'end') { if (s && s.pts.length) out.strokes.push(s); s = null; }
        else if (s && /^[-+0-9.]/.test(w[0])) s.pts.push([+w[0], +w[1], w.length > 2 ? +w[2] : 0.5]);
    }
    return out;
}
function download(bytes, name, type) {
    const a = document.createElement('a');
    a.href = URL.createObjectURL(new Blob([bytes], { type: type || 'application/octet-stream' }));
    a.download = name;
    document.body.appendChild(a);
    a.click();
    setTimeout(() => { URL.revokeObjectURL(a.href); a.remove(); }, 1000);
}
$('save-sketch').onclick = () => download(toTns(), 'sketch.tns', 'text/plain');
$('load-sketch').onchange = async (e) => {
    const f = e.target.files[0];
    if (!f) return;
    try {
        const r = await ask('sketchToTns', { bytes: await f.arrayBuffer(), name: f.name });
        snapshot();
        Object.assign(sketch, fromTns(r.tns));
        redraw();
        status(`${f.name}: ${sketch.strokes.length} strokes on ${sketch.canvasW} x ${sketch.canvasH}`);
    } catch (err) { status(`${f.name}: ${err.message}`); }
};

// ---- styles ----------------------------------------------------------------------------------
let styles = [];
let style = null;        // the loaded style's entry in styles.json (or the user's file)
let styleBytes = null;   // its model file, kept to load it again into a fresh worker (cancel)
async function loadStyle(entry, bytes) {
    status(`loading style ${entry.label}...`);
    if (!bytes) bytes = await (await fetch('styles/' + entry.file)).arrayBuffer();
    const copy = new Uint8Array(bytes.slice(0));
    await ask('loadModel', { bytes: bytes }, [bytes]);
    style = entry;
    styleBytes = copy;
    status(`style: ${entry.label} (${entry.region || 'your model'})`);
}
// styles that are not bundled (a user's file, one learnt in the page) follow the bundled ones in the list
const extraStyles = [];
async function addStyle(entry, bytes) {
    await loadStyle(entry, bytes.slice().buffer);
    extraStyles.push({ entry: entry, bytes: bytes });
    const o = document.createElement('option');
    o.textContent = entry.label;
    $('style').appendChild(o);
    $('style').selectedIndex = $('style').options.length - 1;
}
$('style').onchange = () => {
    const i = $('style').selectedIndex;
    const x = i < styles.length ? null : extraStyles[i - styles.length];
    (x ? loadStyle(x.entry, x.bytes.slice().buffer) : loadStyle(styles[i])).catch((err) => status(err.message));
};
$('own-style').onchange = async (e) => {
    const f = e.target.files[0];
    if (!f) return;
    try { await addStyle({ id: 'own', label: 'yours: ' + f.name, file: f.name, range: null }, new Uint8Array(await f.arrayBuffer())); }
    catch (err) { status(`${f.name}: ${err.message}`); }
};

// ---- results ---------------------------------------------------------------------------------
const view = new View3D($('view'));
let result = null;
let expectedMsPerPixel = 3000 / 65536; // until the first run says otherwise
function showResult(r) {
    result = r;
    const c = document.createElement('canvas');
    c.width = r.width;
    c.height = r.height;
    c.getContext('2d').putImageData(new ImageData(new Uint8ClampedArray(r.rgba), r.width, r.height), 0, 0);
    const shade = $('shade'), sctx = shade.getContext('2d');
    sctx.imageSmoothingEnabled = true;
    sctx.drawImage(c, 0, 0, shade.width, shade.height);
    background = c;
    redraw();
    view.setTerrain(r.terrain, r.width, r.height, r.rgba);
}
async function generate() {
    if (!sketch.strokes.length) { status('draw a ridge or a valley first'); return null; }
    const size = +$('size').value, seed = +$('seed').value || 0;
    $('generate').disabled = true;
    setBusy(1);
    const t0 = performance.now(), expected = expectedMsPerPixel * size * size;
    let libFraction = 0, stage = 'gnn-generate';
    onProgress = (st, f) => { stage = st; libFraction = f; };
    const tick = setInterval(() => {
        const ms = performance.now() - t0;
        // the library reports per tile (maps over 384^2); below that, the time of the last run
        const f = libFraction > 0 ? libFraction : Math.min(0.95, ms / expected);
        bar(f);
        status(`${stage}: ${(ms / 1000).toFixed(1)} s${libFraction > 0 ? '' : ` (~${(expected / 1000).toFixed(1)} s expected)`}`);
    }, 100);
    try {
        const r = await ask('generate', { tns: toTns(), width: size, height: size, seed: seed });
        expectedMsPerPixel = r.ms / (size * size);
        bar(1);
        showResult(r);
        status(`${size} x ${size} in ${(r.seconds).toFixed(2)} s (WebAssembly, 1 thread)\n` +
            `heights ${r.lo.toFixed(1)} .. ${r.hi.toFixed(1)} (${style && style.range ? 'metres' : 'the model\'s units'})`);
        return r;
    } catch (err) {
        bar(0);
        status('generate: ' + err.message);
        throw err;
    } finally {
        clearInterval(tick);
        onProgress = null;
        $('generate').disabled = false;
        setBusy(-1);
    }
}
$('generate').onclick = () => generate().catch(() => {});
$('cancel').onclick = () => {
    status('cancelling: starting a fresh worker...');
    cancel().then(() => status('cancelled; the style is loaded again'), (err) => status('cancel: ' + err.message));
};

for (const b of document.querySelectorAll('button[data-kind]')) {
    b.onclick = async () => {
        if (!result) { status('generate (or load a DEM) first'); return; }
        try {
            const r = await ask('exportTerrain', { kind: +b.dataset.kind, dx: style && style.dx ? style.dx : 0 });
            const name = 'terrain' + r.ext;
            download(r.bytes, name);
            status(`${name}: ${r.bytes.length} bytes` + (r.ext === '.raw' ?
                `\nUnity: set the terrain's height to ${(r.hi - r.lo).toFixed(1)} and lift it by ${r.lo.toFixed(1)}` : ''));
        } catch (err) { status('export: ' + err.message); }
    };
}
$('load-dem').onchange = async (e) => {
    const f = e.target.files[0];
    if (!f) return;
    try {
        const r = await ask('loadTerrain', { bytes: await f.arrayBuffer(), name: f.name });
        showResult(r);
        status(`${f.name}: ${r.width} x ${r.height}, heights ${r.lo.toFixed(1)} .. ${r.hi.toFixed(1)}`);
    } catch (err) { status(`${f.name}: ${err.message}`); }
};

// ---- learning a style in the page (optional in issue 35) ---------------------------------------
let learnt = null;
$('learn').onclick = async () => {
    const f = $('learn-dem').files[0];
    if (!f) { status('choose a DEM file to learn from first'); return; }
    const minutes = Math.max(0.2, +$('learn-minutes').value || 2), lo = +$('learn-lo').value || 0, hi = +$('learn-hi').value || 0;
    $('learn').disabled = $('generate').disabled = true;
    setBusy(1);
    const t0 = performance.now();
    let fraction = 0;
    onProgress = (st, fr) => { fraction = fr; };
    const tick = setInterval(() => {
        bar(fraction);
        status(`learning ${f.name}: ${((performance.now() - t0) / 1000).toFixed(0)} s of ${(minutes * 60).toFixed(0)} s (the page works on; one thread)`);
    }, 250);
    try {
        const r = await ask('train', { bytes: await f.arrayBuffer(), name: f.name, lo: lo, hi: hi, minutes: minutes });
        learnt = { bytes: r.bytes, name: f.name.replace(/\.[^.]*$/, '') + '.tnw' };
        await addStyle({ id: 'learnt', label: 'learnt from ' + f.name, file: learnt.name, range: hi > lo ? [lo, hi] : null }, r.bytes);
        $('save-style').disabled = false;
        bar(1);
        status(`learnt: ${r.summary}\nnow draw and Generate in its style`);
    } catch (err) {
        bar(0);
        status('learn: ' + err.message);
    } finally {
        clearInterval(tick);
        onProgress = null;
        $('learn').disabled = $('generate').disabled = false;
        setBusy(-1);
    }
};
$('save-style').onclick = () => { if (learnt) download(learnt.bytes, learnt.name); };

// ---- start, and the self-test --------------------------------------------------------------
// One 128 x 128 generation of the bundled test sketch (worker.js, warmup: why).
async function warmup() {
    status('warming up the WebAssembly compiler (one 128 x 128 generation)...');
    const tns = await (await fetch('styles/selftest_sketch.tns')).text();
    return (await ask('warmup', { tns: tns, size: 128 })).ms;
}
async function selftest() {
    const out = $('selftest');
    try {
        const spec = await (await fetch('styles/selftest.json')).json();
        const entry = styles.find((s) => s.id === spec.style);
        if (!entry) throw new Error(`style ${spec.style} is not in styles/styles.json`);
        $('style').selectedIndex = styles.indexOf(entry);
        await loadStyle(entry);
        const warmMs = await warmup();
        const r0 = await ask('sketchToTns', { bytes: await (await fetch('styles/' + spec.sketch)).arrayBuffer(), name: spec.sketch });
        Object.assign(sketch, fromTns(r0.tns));
        $('size').value = String(spec.width);
        $('seed').value = String(spec.seed);
        redraw();
        // the generation as the page runs it, but from the .tns text the CLI read (bit for bit)
        const t0 = performance.now();
        const r = await ask('generate', { tns: r0.tns, width: spec.width, height: spec.height, seed: spec.seed });
        const wall = performance.now() - t0;
        showResult(r);
        bar(1);
        const c = await ask('compare', { bytes: await (await fetch('styles/' + spec.reference)).arrayBuffer() });
        // the library's four writers, in WebAssembly: each file starts as its format says
        const magic = { '.png': [0x89, 0x50, 0x4e, 0x47], '.tif': [0x49, 0x49], '.glb': [0x67, 0x6c, 0x54, 0x46] };
        const files = [];
        let exportsOk = true;
        window.studioExports = {};
        for (const kind of [0, 1, 2, 3]) {
            const e = await ask('exportTerrain', { kind: kind, dx: entry.dx || 0 });
            const b = e.bytes, m = magic[e.ext];
            const good = m ? m.every((x, i) => b[i] === x) : b.length === 257 * 257 * 2;
            exportsOk = exportsOk && good;
            files.push(`${e.ext.slice(1)}:${b.length}${good ? '' : '(bad)'}`);
            window.studioExports[e.ext] = Array.from(b);
        }
        // Cancel: a 512^2 generation stopped after 0.3 s fails with 'cancelled', and the fresh
        // worker, with the style loaded again, generates
        let cancelOk = false;
        const big = ask('generate', { tns: r0.tns, width: 512, height: 512, seed: spec.seed }).then(() => 'finished', (e) => e.message);
        await new Promise((res) => setTimeout(res, 300));
        await cancel();
        const after = await ask('generate', { tns: r0.tns, width: 128, height: 128, seed: spec.seed });
        cancelOk = (await big) === 'cancelled' && after.width === 128;
        const ok = c.maxdiff <= 1e-4 && exportsOk && cancelOk;
        out.textContent = `selftest: ${ok ? 'ok' : 'FAIL'} ms=${Math.round(r.seconds * 1000)} maxdiff=${c.maxdiff.toExponential(3)}` +
            ` identical=${c.identical ? 'yes' : 'no'} size=${r.width}x${r.height} style=${spec.style} wall_ms=${Math.round(wall)}` +
            ` warmup_ms=${Math.round(warmMs)} exports=${files.join(',')} cancel=${cancelOk ? 'ok' : 'FAIL'}`;
        status(`self-test: ${r.width} x ${r.height} in ${r.seconds.toFixed(2)} s`);
    } catch (err) {
        out.textContent = 'selftest: FAIL ' + err.message;
    }
    document.body.dataset.selftest = 'done';
}

(async function start() {
    redraw();
    view.draw();
    try {
        styles = await (await fetch('styles/styles.json')).json();
        for (const s of styles) {
            const o = document.createElement('option');
            o.textContent = s.label;
            $('style').appendChild(o);
        }
        if (params.get('selftest') === '1') { await selftest(); return; }
        await loadStyle(styles[0]);
        await warmup();
        status(`style: ${styles[0].label}. Draw ridges (red) and valleys (blue), then Generate.`);
    } catch (err) {
        status('could not start: ' + err.message + ' (serve the folder: python3 -m http.server -d studio)');
        if (params.get('selftest') === '1') { $('selftest').textContent = 'selftest: FAIL ' + err.message; document.body.dataset.selftest = 'done'; }
    }
})();
