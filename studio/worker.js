// terrainnet studio's worker: terrainnet compiled to WebAssembly (terrainnet.js / .wasm, built by
// `make studio` from studio.c) runs here, so the page stays responsive while it works.
// Messages in: {id, cmd, ...}; out: {id, ok, error?, ...} and {progress, stage} while generating.
/* global createTerrainnet */
importScripts('terrainnet.js');

let M = null;
const ready = createTerrainnet({
    print: (t) => console.log('[wasm] ' + t),
    printErr: (t) => console.warn('[wasm] ' + t),
}).then((m) => {
    M = m;
    M.FS.mkdir('/in');
    M.FS.mkdir('/out');
});

// called from C (studio.c's EM_JS) with the library's progress reports
self.studioProgress = (stage, fraction) => postMessage({ progress: fraction, stage: stage });

function call(name, ret, types, args) {
    return M.ccall(name, ret, types, args);
}
function check(rc) {
    if (rc !== 0) throw new Error(call('studio_error', 'string', [], []));
}
function take(path) { // a file the library wrote, removed from the in-memory file system
    const bytes = M.FS.readFile(path);
    M.FS.unlink(path);
    return bytes;
}
function terrainMessage() {
    const w = call('studio_width', 'number', [], []), h = call('studio_height', 'number', [], []);
    const ptr = call('studio_terrain', 'number', [], []);
    const terrain = new Float32Array(M.HEAPF32.buffer, ptr, w * h).slice();
    const rgbaPtr = call('studio_hillshade', 'number', [], []);
    if (!rgbaPtr) throw new Error(call('studio_error', 'string', [], []));
    const rgba = new Uint8ClampedArray(M.HEAPU8.buffer, rgbaPtr, 4 * w * h).slice();
    return {
        width: w, height: h, terrain: terrain, rgba: rgba,
        lo: call('studio_lo', 'number', [], []), hi: call('studio_hi', 'number', [], []),
        seconds: call('studio_seconds', 'number', [], []),
    };
}

const commands = {
    // a .tnw model (bytes)
    loadModel(msg) {
        M.FS.writeFile('/in/model.tnw', new Uint8Array(msg.bytes));
        check(call('studio_load_model', 'number', ['string'], ['/in/model.tnw']));
        return {};
    },
    // a .tns text or a drawn image -> .tns text (what the page edits)
    sketchToTns(msg) {
        const ext = (msg.name.match(/\.[A-Za-z0-9]+$/) || ['.tns'])[0].toLowerCase();
        const path = '/in/drawing' + ext;
        M.FS.writeFile(path, new Uint8Array(msg.bytes));
        check(call('studio_sketch_to_tns', 'number', ['string', 'string'], [path, '/out/sketch.tns']));
        M.FS.unlink(path);
        return { tns: new TextDecoder().decode(take('/out/sketch.tns')) };
    },
    // the sketch (.tns text) -> terrain, hillshade, range, seconds
    generate(msg) {
        M.FS.writeFile('/in/sketch.tns', msg.tns);
        const t0 = performance.now();
        check(call('studio_generate', 'number', ['string', 'number', 'number', 'number'],
            ['/in/sketch.tns', msg.width, msg.height, msg.seed]));
        const out = terrainMessage();
        out.ms = performance.now() - t0;
        return out;
    },
    // a small generation right after the page loads: the browser compiles WebAssembly with a
    // quick baseline compiler first and optimises the functions that run hot, so the user's
    // first terrain would otherwise run mostly unoptimised (measured: 5.5 s instead of 2.8 s)
    warmup(msg) {
        M.FS.writeFile('/in/warmup.tns', msg.tns);
        const t0 = performance.now();
        check(call('studio_generate', 'number', ['string', 'number', 'number', 'number'], ['/in/warmup.tns', msg.size, msg.size, 1]));
        call('studio_clear', null, [], []);
        return { ms: performance.now() - t0 };
    },
    // learns a style from a DEM file in the page (studio_train: gnn-train's recipe, a time budget)
    train(msg) {
        const path = '/in/example' + ((msg.name.match(/\.[A-Za-z0-9]+$/) || ['.png'])[0].toLowerCase());
        M.FS.writeFile(path, new Uint8Array(msg.bytes));
        check(call('studio_train', 'number', ['string', 'number', 'number', 'number', 'string'],
            [path, msg.lo, msg.hi, msg.minutes, '/out/model.tnw']));
        M.FS.unlink(path);
        return { bytes: take('/out/model.tnw'), summary: call('studio_error', 'string', [], []) };
    },
    // a DEM file to view and export
    loadTerrain(msg) {
        const path = '/in/terrain' + ((msg.name.match(/\.[A-Za-z0-9]+$/) || ['.png'])[0].toLowerCase());
        M.FS.writeFile(path, new Uint8Array(msg.bytes));
        check(call('studio_load_terrain', 'number', ['string'], [path]));
        M.FS.unlink(path);
        return terrainMessage();
    },
    // the library's writers: kind 0 PNG16, 1 GeoTIFF, 2 .glb, 3 Unity RAW
    exportTerrain(msg) {
        const ext = ['.png', '.tif', '.glb', '.raw'][msg.kind];
        const path = '/out/terrain' + ext;
        check(call('studio_export', 'number', ['string', 'number', 'number'], [path, msg.kind, msg.dx || 0]));
        return {
            bytes: take(path), ext: ext,
            lo: call('studio_lo', 'number', [], []), hi: call('studio_hi', 'number', [], []),
        };
    },
    // the self-test's comparison with a reference terrain (the native CLI's .pfm)
    compare(msg) {
        M.FS.writeFile('/in/reference.pfm', new Uint8Array(msg.bytes));
        const p = M._malloc(4);
        const d = call('studio_compare', 'number', ['string', 'number'], ['/in/reference.pfm', p]);
        const identical = M.HEAP32[p >> 2];
        M._free(p);
        if (d < 0) throw new Error(call('studio_error', 'string', [], []));
        return { maxdiff: d, identical: identical !== 0 };
    },
};

onmessage = (e) => {
    const msg = e.data;
    ready.then(() => {
        const out = commands[msg.cmd](msg);
        out.id = msg.id;
        out.ok = true;
        const transfer = [];
        for (const k of ['terrain', 'rgba', 'bytes']) if (out[k]) transfer.push(out[k].buffer);
        postMessage(out, transfer);
    }).catch((err) => postMessage({ id: msg.id, ok: false, error: String(err && err.message || err) }));
};
